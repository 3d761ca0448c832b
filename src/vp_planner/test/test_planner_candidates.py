"""Planning among candidate views: N of M given poses, for every method."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vp_planner.candidates import CandidateSpace, evenly_spaced, neighbours
from vp_planner.methods import CANDIDATE_METHODS
from vp_planner.optimizers import plan_views
from vp_planner.request import InvalidCandidatesError, PlanRequest
from vp_planner.reward_models import make_reward
from vp_scene.camera import CameraModel


def ring(m: int, radius: float, height: float, target=(0.0, 0.0, 1.0), phase: float = 0.0) -> np.ndarray:
    """m cameras evenly on a horizontal circle, all looking at ``target`` (a rig's stops)."""
    a = phase + 2 * np.pi * np.arange(m) / m
    c = np.stack([radius * np.cos(a), radius * np.sin(a), np.full(m, height)], axis=1)
    return np.concatenate([c, np.asarray(target) - c], axis=1)


@pytest.fixture(scope="module")
def prior(realizations) -> np.ndarray:
    return realizations[:1, ::3]


@pytest.mark.parametrize("method", CANDIDATE_METHODS)
def test_every_method_chooses_n_of_the_candidates(method, prior) -> None:
    """The plan is N distinct candidates, its cameras those candidates in the order of
    ``selected``, its reward the reward model's on them, never beaten by an evaluation it made."""
    cand = ring(24, 2.0, 1.2)[np.random.default_rng(1).permutation(24)]  # in no particular order
    res = plan_views(PlanRequest.of(method, 5, evaluations=16, initial_evaluations=8, seed=2, candidates=cand),
                     prior)
    assert len(res.selected) == 5 == len(set(res.selected)) and all(0 <= i < 24 for i in res.selected)
    np.testing.assert_array_equal(res.cameras, cand[res.selected])
    assert res.reward == pytest.approx(float(make_reward("coverage", prior)(cand[res.selected][None])[0]), abs=1e-9)
    assert res.reward == pytest.approx(float(res.rewards.max())) and not res.stopped
    assert 1 <= res.evaluations <= 16


def test_circle_is_evenly_spaced_and_arc_is_neighbours(prior) -> None:
    """circle: every M/N-th candidate of a ring; arc: N consecutive ones (their azimuths about the
    prior's centre), whatever the candidates' order in the list."""
    order = np.random.default_rng(0).permutation(60)
    cand = ring(60, 2.0, 1.2)[order]
    space = CandidateSpace(cand, 6, prior)
    pos = order  # the ring position of every list index
    def gaps(subset) -> list:  # the circular gaps between the chosen ring positions, sorted
        p = np.sort(pos[subset])
        return sorted(np.diff(np.append(p, p[0] + 60)).tolist())

    assert all(gaps(s) == [10] * 6 for s in evenly_spaced(space, 100))
    assert all(gaps(s) == [1] * 5 + [55] for s in neighbours(space, 100))
    assert len(neighbours(space, 100)) == 60 and len(neighbours(space, 7)) == 7  # every start, or the budget's
    res = plan_views(PlanRequest.of("circle", 6, evaluations=100, candidates=cand), prior)
    assert gaps(res.selected) == [10] * 6 and res.evaluations == 10  # the 10 distinct phases


def test_bad_candidates_are_named_errors(prior) -> None:
    cand = ring(8, 2.0, 1.2)
    for values, text in ((dict(method="lawnmower"), "no candidates mode"),
                         (dict(num_cameras=9), "9 cameras cannot be chosen among 8"),
                         (dict(candidates=np.where(np.eye(8, 6) > 0, np.nan, cand)), "not finite"),
                         (dict(candidates=cand[:, :5]), "shape"),
                         (dict(candidates=np.zeros((8, 6))), "zero viewing direction")):
        with pytest.raises(InvalidCandidatesError, match=text):
            PlanRequest.from_dict({"method": "circle", "num_cameras": 4, "candidates": cand, **values})
    q = PlanRequest.of("random", 4, evaluations=3, candidates=cand)
    assert PlanRequest.from_dict(q.as_dict()) == q  # the flat form (JSON records) carries the candidates


def test_the_coverage_reward_scores_wide_gaps_low() -> None:
    """Few views can fail where more work (10 real views every 36 degrees registered 2
    of 10): the matching window scores a ring whose neighbours are 36 degrees apart well below one
    18 degrees apart, and 60 degrees apart (6 views: beyond the window no pair links a view to
    another, each is a part of its own, which the registration scores 0)."""
    rng = np.random.default_rng(0)
    plant = np.concatenate([np.stack([0.01 * rng.standard_normal(500), 0.01 * rng.standard_normal(500),
                                      rng.uniform(0.0, 0.4, 500)], axis=1),
                            rng.uniform([-0.08, -0.08, 0.1], [0.08, 0.08, 0.3], (500, 3))])[None]
    cand = ring(60, 0.5, 0.2, target=(0.0, 0.0, 0.2))
    fov = 2 * math.atan(720 / 1158.8)  # the dev scan's camera
    reward = make_reward("coverage", plant, fov, image=CameraModel(1440, 1080, fov))
    r = {n: float(reward(cand[:: 60 // n][None])[0]) for n in (6, 10, 20)}
    assert r[20] > 0.95 and r[10] < 0.85 * r[20] and r[6] <= 0.5 * r[10], r
    assert r[6] == 0.0, r
