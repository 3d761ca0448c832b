"""The shell-and-target search space, feasibility, and the objective wrapper."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from vp_planner.designs import random_plans, structured_plans
from vp_planner.reward import noisy_reward
from vp_planner.reward_models import make_reward
from vp_planner.objective import Objective
from vp_planner.space import NoFeasiblePlanError, PlanningCancelled, ViewSpace


@pytest.fixture(scope="module")
def space4(realizations: np.ndarray) -> ViewSpace:
    return ViewSpace(realizations, 4)


def test_decode_shapes_and_kinds(space4: ViewSpace) -> None:
    assert space4.dim == 24
    U = np.random.default_rng(0).random((7, 24))
    cams = space4.decode(U)
    assert isinstance(cams, np.ndarray) and cams.shape == (7, 4, 6)
    t = space4.decode(torch.as_tensor(U))
    assert isinstance(t, torch.Tensor) and t.shape == (7, 4, 6)
    np.testing.assert_allclose(t.numpy(), cams)
    assert space4.decode(U[0]).shape == (4, 6)
    with pytest.raises(ValueError):
        space4.decode(np.zeros((2, 23)))


def test_altitude_and_standoff_hold_by_construction(space4: ViewSpace) -> None:
    rng = np.random.default_rng(1)
    U = rng.random((3000, 24))
    U[:50] = rng.integers(0, 2, size=(50, 24))  # the cube's corners too
    cams = space4.decode(U).reshape(-1, 6)
    assert np.all(cams[:, 2] >= space4.min_altitude - 1e-12)
    d, _ = space4.tree.query(cams[:, :3])
    assert d.min() >= space4.min_standoff - 1e-9
    assert np.all(np.linalg.norm(cams[:, 3:], axis=1) > 0)
    # targets lie inside the scene box
    tgt = cams[:, :3] + cams[:, 3:]
    assert np.all(tgt >= space4.extent.lo - 1e-9) and np.all(tgt <= space4.extent.hi + 1e-9)


def test_random_plans_mostly_feasible_and_see_the_plant(space4: ViewSpace, realizations: np.ndarray) -> None:
    """Most random plans of this space are feasible and score > 0; of a naive box, few do."""
    rng = np.random.default_rng(2)
    n = 400
    U = rng.random((n, 24))
    ok = space4.feasible(U)
    assert ok.dtype == bool and ok.shape == (n,)
    assert ok.mean() > 0.8
    r = noisy_reward(space4.decode(U[ok]), realizations)
    frac_space = float((r > 0).mean())
    assert frac_space > 0.9
    # naive box: positions in the scene box grown by 1.5 m, v in [-1, 1]^3
    lo = space4.extent.lo - 1.5
    hi = space4.extent.hi + 1.5
    lo[2] = space4.min_altitude
    cams = np.concatenate([lo + (hi - lo) * rng.random((n, 4, 3)), rng.uniform(-1, 1, (n, 4, 3))], axis=-1)
    rb = noisy_reward(cams, realizations) * space4.feasible(cams)
    frac_box = float((rb > 0).mean())
    assert frac_box < 0.5 * frac_space


def test_feasible_detects_violations(space4: ViewSpace) -> None:
    U = random_plans(space4, 5, np.random.default_rng(3))
    cams = space4.decode(U)
    assert space4.feasible(cams).all() and space4.feasible(U).all()
    assert space4.feasible(torch.as_tensor(U)).dtype == torch.bool
    assert space4.feasible(cams[0]) is True
    low = cams.copy()
    low[0, 1, 2] = 0.1  # below min_altitude
    near = cams.copy()
    near[1, 2, :3] = space4.realizations[0, 10] + [0.1, 0, 0]  # 0.1 m from a point
    crowd = cams.copy()
    crowd[2, 3, :3] = crowd[2, 0, :3] + [0.2, 0, 0]  # 0.2 m from another camera
    zero_v = cams.copy()
    zero_v[3, 0, 3:] = 0.0
    nan = cams.copy()
    nan[4, 0, 0] = np.nan
    bad = np.stack([low[0], near[1], crowd[2], zero_v[3], nan[4]])
    assert not space4.feasible(bad).any()
    with pytest.raises(ValueError):
        space4.feasible(np.zeros((2, 5, 6)))


def test_sample_and_structured(space4: ViewSpace, realizations: np.ndarray) -> None:
    rng = np.random.default_rng(4)
    U = random_plans(space4, 30, rng)
    assert U.shape == (30, 24) and space4.feasible(U).all()
    assert np.all((U >= 0) & (U <= 1))
    S = structured_plans(space4)
    assert len(S) >= 4 and space4.feasible(S).all()
    rs = noisy_reward(space4.decode(S), realizations)
    rr = noisy_reward(space4.decode(U), realizations)
    assert np.median(rs) > np.median(rr)
    crowded = ViewSpace(realizations, 4, min_separation=100.0)
    with pytest.raises(NoFeasiblePlanError, match="feasible"):
        random_plans(crowded, 3, rng, max_tries=3)


def test_objective_records_and_cancels(space4: ViewSpace, realizations: np.ndarray) -> None:
    calls = []

    def cb(done, total, best, weights):
        calls.append((done, total, best))
        return done < 6

    obj = Objective(space4, total=8, callback=cb)
    U = random_plans(space4, 3, np.random.default_rng(9))   # 3 plans that score (most random plans fall apart)
    infeasible = U[:1].copy()
    infeasible[0, 6:12] = infeasible[0, 0:6]  # two cameras at the same place
    assert not space4.feasible(infeasible).any()
    vals = obj(np.concatenate([U, infeasible]))
    assert isinstance(vals, np.ndarray) and vals.shape == (4,)
    assert vals[3] == 0.0 and np.all(vals[:3] > 0)
    expected = make_reward(space4.reward_model, realizations)(space4.decode(U))
    np.testing.assert_allclose(vals[:3], expected, atol=1e-6)
    assert obj.count == 4 and [c[0] for c in calls] == [1, 2, 3, 4]
    tv = obj(torch.as_tensor(U[:1]))
    assert isinstance(tv, torch.Tensor)
    with pytest.raises(PlanningCancelled):
        obj(U)  # the callback returns False at the 6th evaluation
    assert obj.cancelled and obj.count == 6
    tr = obj.trace()
    assert len(tr) == 6 and np.all(np.diff(tr) >= 0) and tr[-1] == pytest.approx(obj.best_value)
    assert space4.feasible(obj.best_cameras())
    full = Objective(space4, total=1)
    full(U[:1])
    with pytest.raises(RuntimeError):
        full(U[:1])


def test_bad_space_arguments(realizations: np.ndarray) -> None:
    with pytest.raises(ValueError):
        ViewSpace(realizations, 1)
    with pytest.raises(ValueError):
        ViewSpace(np.zeros((2, 0, 3)), 4)
    bad = realizations.copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(ValueError):
        ViewSpace(bad, 4)
    with pytest.raises(ValueError):
        ViewSpace(realizations, 4, min_standoff=-1.0)
    assert math.isfinite(ViewSpace(realizations[0], 3).shell_depth)
