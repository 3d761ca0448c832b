"""Fields: planning by parts (vp_planner.parts), the lawnmower survey, and the space's obstacle and
fixed-camera rules that planning by parts rests on."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vp_planner.baselines import CircleFamily
from vp_planner.bo_planning import field_starts
from vp_planner.designs import structured_plans
from vp_planner.optimizers import plan_views
from vp_planner.request import InvalidNumCamerasError, PlanRequest
from vp_planner.parts import JointSpace, allocate_cameras, auto_parts, partition
from vp_planner.patterns import footprint, lawnmower
from vp_planner.reward_models import make_reward
from vp_planner.space import ViewSpace
from vp_scene.camera import CameraModel, project, rotation_matrix


@pytest.fixture(scope="module")
def two_plants(plant_row):
    return plant_row([-1.5, 1.5])


def test_partition_finds_the_plants_in_order_along_the_field(two_plants, plant_row) -> None:
    R, plant = two_plants
    labels = partition(R, 2, seed=0)
    assert np.array_equal(labels, plant)          # the left plant is part 0
    R3, plant3 = plant_row([2.0, -2.0, 0.0], n=200)   # listed out of order
    labels3 = partition(R3, 3, seed=1)
    order = {int(plant3[i]): int(labels3[i]) for i in range(len(plant3))}
    assert order == {1: 0, 2: 1, 0: 2}            # x = -2, 0, 2
    assert not partition(R, 1).any()
    with pytest.raises(ValueError, match="parts must be"):
        partition(R, 0)


def test_cameras_are_allocated_in_proportion_with_a_pair_each() -> None:
    assert allocate_cameras([100, 100, 100], 12).tolist() == [4, 4, 4]
    assert allocate_cameras([300, 100], 8).tolist() == [5, 3]
    assert allocate_cameras([1000, 1], 5).tolist() == [3, 2]
    assert allocate_cameras([5, 3, 2], 16).sum() == 16
    with pytest.raises(ValueError, match="cannot give 3 parts"):
        allocate_cameras([1, 1, 1], 5)


def test_automatic_parts_keep_a_plant_whole_and_four_cameras_a_part(two_plants, realizations, plant_row) -> None:
    R, _ = two_plants
    assert auto_parts(R, 8) == 2
    assert auto_parts(R, 7) == 1        # 4 cameras a part
    assert auto_parts(realizations, 12) == 1   # one plant is never cut in two
    assert auto_parts(plant_row([0.0, 1.3, 2.6, 3.9], n=100)[0], 16) == 3   # about 5 m: 1.2 m a part


def test_obstacles_and_fixed_cameras_are_feasibility_rules(two_plants) -> None:
    R, plant = two_plants
    left = R[:, plant == 0]
    cam = np.array([[1.5, 0.0, 2.2, 0.0, 0.0, -1.0], [-1.5, 1.2, 1.0, 0.0, -1.0, 0.0]])  # above the right plant
    assert ViewSpace(left, 2, min_separation=0.5).feasible(cam)
    assert not ViewSpace(left, 2, min_separation=0.5, obstacles=R).feasible(cam)
    ok = np.array([[-1.5, 1.5, 1.0, 0.0, -1.0, 0.0], [-1.5, -1.5, 1.0, 0.0, 1.0, 0.0]])
    assert ViewSpace(left, 2, obstacles=R, fixed_positions=[[-1.5, 2.5, 1.0]]).feasible(ok)
    assert not ViewSpace(left, 2, obstacles=R, fixed_positions=[[-1.5, 1.8, 1.0]]).feasible(ok)
    with pytest.raises(ValueError, match="fixed_positions"):
        ViewSpace(left, 2, fixed_positions=[[0.0, 0.0]])


def test_the_joint_space_decodes_each_block_in_its_part(two_plants) -> None:
    R, plant = two_plants
    parts = [ViewSpace(R[:, plant == g], 2, obstacles=R) for g in (0, 1)]
    joint = JointSpace(ViewSpace(R, 4), parts)
    U = np.random.default_rng(0).random((5, 24))
    cams = joint.decode(U)
    np.testing.assert_allclose(cams[:, :2], parts[0].decode(U[:, :12]))
    np.testing.assert_allclose(cams[:, 2:], parts[1].decode(U[:, 12:]))
    assert joint.periodic.tolist() == ViewSpace(R, 4).periodic.tolist()
    assert np.array_equal(joint.feasible(U), ViewSpace(R, 4)._feasible_cameras(cams))


def test_egp_by_parts_plans_every_plant_and_counts_every_evaluation(two_plants) -> None:
    """Two plants 3 m apart, 4 cameras in 2 parts: each part's 2 cameras are planned on its own
    plant, then jointly. The plan is feasible for the whole field, every plant is seen by at least
    one pair, and the budget is 2 x 12 + 6 evaluations, the parts' first (no complete plan yet:
    trace 0), then the whole field's starts (2 of the 6: the tuned circle's ring, a structured
    plan) and the joint refinement's."""
    R, plant = two_plants
    seen = []
    res = plan_views(PlanRequest.of("egp", 4, evaluations=12, initial_evaluations=6, seed=0, parts=2), R,
                     callback=lambda done, total, best, w: seen.append((done, total, best)) is None)
    assert res.evaluations == 30 and not res.stopped and res.cameras.shape == (4, 6)
    assert [s[0] for s in seen] == list(range(1, 31)) and all(s[1] == 30 for s in seen)
    assert ViewSpace(R, 4).feasible(res.cameras)
    assert [p["cameras"] for p in res.parts] == [2, 2] and all(p["evaluations"] == 12 for p in res.parts)
    assert not res.trace[:24].any() and res.trace[-1] > 0 and np.all(np.diff(res.trace[24:]) >= 0)
    assert res.reward == pytest.approx(float(make_reward("coverage", R)(res.cameras[None])[0]), abs=1e-6)
    # evaluations 25-26: the whole field's starts, scored on the whole field: the circle family's
    # ring (a grid of one cell: mid-height, mid-radius), then the first structured plan
    space = ViewSpace(R, 4)
    fam = CircleFamily(space)
    whole = np.stack([fam.plan(0.5, 0.5 * (fam.h_lo + fam.h_hi)), space.decode(structured_plans(space, 1))[0]])
    np.testing.assert_allclose(field_starts(space, 2)[1], whole, atol=1e-12)
    np.testing.assert_allclose(res.rewards[24:26], make_reward("coverage", R)(whole), atol=1e-6)
    image = CameraModel()
    for g in (0, 1):
        pts = R[0, plant == g]
        views = [np.mean(project(pts, c, image.width, image.height, image.fov)[1]) for c in res.cameras]
        assert sum(v > 0.5 for v in views) >= 2, views   # a pair sees most of the plant


def test_cancel_while_planning_a_part(two_plants) -> None:
    R, _ = two_plants
    res = plan_views(PlanRequest.of("egp", 4, evaluations=12, initial_evaluations=6, parts=2), R,
                     callback=lambda done, total, best, w: done < 5)
    assert res.stopped and res.evaluations == 5 and res.cameras.shape == (0, 6)


def test_too_many_parts_for_the_cameras(two_plants) -> None:
    R, _ = two_plants
    with pytest.raises(InvalidNumCamerasError, match="parts = 3 needs at least 6 cameras"):
        plan_views(PlanRequest.of("egp", 4, evaluations=12, initial_evaluations=6, parts=3), R)
    with pytest.raises(ValueError, match="parts must be >= 0"):
        plan_views(PlanRequest.of("egp", 4, evaluations=12, initial_evaluations=6, parts=-1), R)


# ---------------------------------------------------------------------- lawnmower
def test_footprint_of_a_nadir_and_a_tilted_camera() -> None:
    image = CameraModel(2000, 1500, math.pi / 2)
    along, across = footprint(2.0, image, 0.0)
    assert along == pytest.approx(2 * 2.0 * 0.75) and across == pytest.approx(4.0)
    along_t, across_t = footprint(2.0, image, math.radians(30))
    b = math.atan(0.75)
    assert along_t == pytest.approx(2.0 * (math.tan(math.radians(30) + b) - math.tan(math.radians(30) - b)))
    assert across_t == pytest.approx(4.0 / math.cos(math.radians(30)))
    with pytest.raises(ValueError, match="does not meet the ground"):
        footprint(2.0, image, math.radians(60))


def test_a_lawnmower_survey_covers_the_field_with_the_overlap() -> None:
    """Every point of the field box (on the canopy plane) lies in at least one image, neighbouring
    images overlap by at least the set fraction, nadir cameras look straight down."""
    image = CameraModel(2000, 1500, math.pi / 2)
    lo, hi, top, d, o = np.array([-3.0, -0.5]), np.array([3.0, 0.5]), 2.0, 1.5, 0.6
    cams = lawnmower(lo, hi, top, d, 10, image, o)
    assert cams is not None and cams.shape == (10, 6)
    np.testing.assert_allclose(cams[:, 2], top + d)
    np.testing.assert_allclose(cams[:, 3:], np.tile([0.0, 0.0, -1.0], (10, 1)))
    along, _ = footprint(d, image)
    xs = np.sort(cams[:, 0])
    assert np.all(np.diff(xs) <= (1 - o) * along + 1e-9)
    eps = 1e-6   # the outer footprints end exactly at the box's edges
    grid = np.stack(np.meshgrid(np.linspace(lo[0] + eps, hi[0] - eps, 40),
                                np.linspace(lo[1] + eps, hi[1] - eps, 9)), -1).reshape(-1, 2)
    pts = np.concatenate([grid, np.full((len(grid), 1), top)], axis=1)
    seen = np.zeros(len(pts), bool)
    for c in cams:
        seen |= project(pts, c, image.width, image.height, image.fov)[1]
    assert seen.all()
    assert lawnmower(lo, hi, top, 0.3, 10, image, o) is None   # too low: 10 images cannot cover it


def test_oblique_survey_flies_back_and_forth(two_plants) -> None:
    """A tilted survey: lines flown in opposite directions look from opposite sides, every optical
    axis meets the canopy plane inside the field box."""
    image = CameraModel(2000, 1500, math.pi / 2)
    lo, hi, top = np.array([-5.0, -4.0]), np.array([5.0, 4.0]), 2.0
    cams = lawnmower(lo, hi, top, 3.0, 8, image, 0.5, tilt=math.radians(30))   # 2 lines of 4
    assert cams is not None and cams.shape == (8, 6)
    v = cams[:, 3:] / np.linalg.norm(cams[:, 3:], axis=1, keepdims=True)
    np.testing.assert_allclose(np.degrees(np.arccos(-v[:, 2])), 30.0)
    assert {int(np.sign(x)) for x in v[:, 0]} == {-1, 1}
    hit = cams[:, :2] + (cams[:, 2:3] - top) / -v[:, 2:3] * v[:, :2]
    assert np.all(hit >= lo - 1e-9) and np.all(hit <= hi + 1e-9)
    y_b = rotation_matrix(cams[:, 3:])[..., 1]        # the image's width axis (vp_scene.camera)
    np.testing.assert_allclose(y_b[:, 0], 0.0, atol=1e-12)   # across the track (lines along x)


def test_lawnmower_method_is_one_feasible_survey(two_plants) -> None:
    R, _ = two_plants
    seen = []
    res = plan_views(PlanRequest.of("lawnmower", 6, evaluations=50), R,
                     callback=lambda done, total, *_: seen.append((done, total)))
    assert res.evaluations == 1 and not res.stopped and res.cameras.shape == (6, 6)
    assert seen == [(1, 1)]                       # its progress says 1 of 1, not 1 of 50
    space = ViewSpace(R, 6)
    assert space.feasible(res.cameras)
    assert np.all(res.cameras[:, 2] >= R[..., 2].max() + 0.5 - 1e-9)
    lower = res.cameras.copy()
    lower[:, 2] -= 0.05
    assert not space.feasible(lower) or lawnmower(space.extent.lo[:2], space.extent.hi[:2], R[..., 2].max(),
                                                  float(lower[0, 2] - R[..., 2].max()), 6, space.image, 0.7,
                                                  min_spacing=0.5) is None   # the lowest such survey
    with pytest.raises(ValueError, match="overlap"):
        plan_views(PlanRequest.of("lawnmower", 6, lawnmower_overlap=1.0), R)
    with pytest.raises(ValueError, match="tilt"):
        plan_views(PlanRequest.of("lawnmower", 6, lawnmower_tilt=math.radians(70)), R)


def test_the_field_starts_hold_the_tuned_circles_grid(two_plants) -> None:
    """Planning by parts scores the circle family's rings first (the grid the tuned circle
    searches, about half of the starts: 3 x 3 of 20), then the structured plans; every one a
    plan of the whole field's N cameras; none for a count of 0."""
    R, _ = two_plants
    space = ViewSpace(R, 6)
    U, cams = field_starts(space, 20)
    fam = CircleFamily(space)
    rings = np.array([fam.plan(a, h) for a, h in fam.grid(10)])
    structured = space.decode(structured_plans(space, 11))      # the infeasible ones dropped
    assert len(rings) == 9 and U.shape == (9 + len(structured), space.dim) and len(cams) == len(U) <= 20
    np.testing.assert_allclose(cams[:9], rings, atol=1e-12)
    np.testing.assert_allclose(cams[9:], structured, atol=1e-12)
    assert field_starts(space, 0)[0].shape == (0, space.dim)
