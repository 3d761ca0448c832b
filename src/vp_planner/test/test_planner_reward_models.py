"""Reward models: each ingredient of ``coverage`` on hand-built cases, and ``paper`` = eqs. 2-7."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from vp_planner.reward import noisy_reward
from vp_planner.reward_models import (DEFAULT_REWARD_MODEL, REGISTRY, REWARD_MODELS, CoverageParams,
                                      check_reward_model, coverage_reward, make_reward, model_parts, placement_error,
                                      point_coverage, reward_model, view_graph, view_graph_factor, within_tau)
from vp_scene.camera import CameraModel, look_at

IMAGE = CameraModel(2000, 1500, math.pi / 2)
ALL_ON = CoverageParams(max_points=0)
#: every ingredient but the registration (the view graph's tests: its factor alone)
NO_REGISTRATION = replace(ALL_ON, registration=False)


def pair_at(distance: float, half_angle_deg: float, target=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Two cameras at ``distance`` from ``target``, +-half_angle in azimuth, looking at it."""
    t = np.asarray(target, float)
    a = np.radians([-half_angle_deg, half_angle_deg])
    c = t + distance * np.stack([np.cos(a), np.sin(a), np.zeros(2)], axis=1)
    return look_at(c, np.broadcast_to(t, c.shape))


def grid_patch(x: float, half: float = 0.05, n: int = 11, z: float = 1.0) -> np.ndarray:
    """A square patch of points in the plane x = const (facing +x), centred at (x, 0, z)."""
    s = np.linspace(-half, half, n)
    yy, zz = np.meshgrid(s, s)
    return np.stack([np.full(yy.size, x), yy.ravel(), z + zz.ravel()], axis=1)


def test_model_names() -> None:
    assert set(REWARD_MODELS) == {"paper", "coverage", "coverage-graph"} and DEFAULT_REWARD_MODEL in REWARD_MODELS
    assert check_reward_model("paper") == "paper"
    with pytest.raises(ValueError, match="unknown reward model"):
        check_reward_model("magic")
    with pytest.raises(ValueError, match="unknown reward model 'magic'; one of paper, coverage, coverage-graph"):
        reward_model("magic")


def test_the_registry_says_what_each_model_is_and_makes_it() -> None:
    """Every name of REWARD_MODELS is an entry of REGISTRY; the coverage family takes CoverageParams
    (coverage-graph with the view graph on, whatever they say), the paper model none."""
    assert tuple(m.name for m in REGISTRY) == REWARD_MODELS and all(m.summary for m in REGISTRY)
    assert reward_model("paper").params(ALL_ON) is None
    assert reward_model("coverage").params(ALL_ON) == ALL_ON
    assert reward_model("coverage-graph").params(ALL_ON) == replace(ALL_ON, view_graph=True)
    pts = blob()
    cams = ring_at(2.0, [0, 12, 24, 36])
    graph = make_reward(("coverage-graph", NO_REGISTRATION), pts, image=IMAGE)(cams[None])[0]
    assert graph == pytest.approx(coverage_reward(cams, pts, replace(NO_REGISTRATION, view_graph=True, max_points=0),
                                                  IMAGE), abs=1e-6)


def test_paper_model_is_eqs_2_to_7() -> None:
    rng = np.random.default_rng(0)
    R = rng.normal(size=(3, 200, 3)) * 0.3 + np.array([0, 0, 1.0])
    cams = np.stack([pair_at(2.0, 10.0), pair_at(2.5, 20.0)])
    got = make_reward("paper", R)(cams)
    np.testing.assert_allclose(got, noisy_reward(cams, R), atol=1e-14)


def test_point_behind_a_wall_is_not_counted() -> None:
    """Self-occlusion: a patch hidden behind a nearer wall of points gets no coverage."""
    wall = grid_patch(0.0, half=0.3, n=31)        # a dense wall at x = 0
    hidden = grid_patch(-0.5, half=0.05, n=5)     # a small patch behind it (seen from +x)
    pts = np.concatenate([wall, hidden])[None]
    cams = pair_at(2.0, 8.0, target=(0.0, 0.0, 1.0))
    with_occ = point_coverage(cams, pts, ALL_ON, IMAGE)[0, len(wall):]
    without = point_coverage(cams, pts, replace(ALL_ON, occlusion=False), IMAGE)[0, len(wall):]
    assert np.all(with_occ == 0.0)
    assert np.all(without > 0.5)
    # the wall itself stays covered
    assert point_coverage(cams, pts, ALL_ON, IMAGE)[0, :len(wall)].mean() > 0.9


def test_far_camera_scores_less_once_resolution_counts() -> None:
    pts = grid_patch(0.0, half=0.05)[None]
    near, far = pair_at(1.5, 8.0), pair_at(6.0, 8.0)
    r_near = coverage_reward(near, pts, ALL_ON, IMAGE)
    r_far = coverage_reward(far, pts, ALL_ON, IMAGE)
    assert r_far < 0.5 * r_near
    no_res = replace(ALL_ON, resolution=False)
    assert coverage_reward(far, pts, no_res, IMAGE) == pytest.approx(coverage_reward(near, pts, no_res, IMAGE),
                                                                   abs=1e-6)


def test_identical_pairs_do_not_double_a_points_score() -> None:
    """Saturation: a point a pair fully covers stays at 1 when an identical pair is added."""
    pts = grid_patch(0.0, half=0.02, n=3)[None]
    one = pair_at(1.5, 8.0)
    two = np.concatenate([one, one + np.array([0.0, 0.0, 1e-6, 0, 0, 0])])  # the same pair twice
    cov_one = point_coverage(one, pts, ALL_ON, IMAGE)
    cov_two = point_coverage(two, pts, ALL_ON, IMAGE)
    np.testing.assert_allclose(cov_one, 1.0, atol=1e-6)
    np.testing.assert_allclose(cov_two, 1.0, atol=1e-6)
    # without saturation the score is a mean over pairs: the point is not counted once per pair
    cov_sum = point_coverage(two, pts, replace(ALL_ON, saturation=False), IMAGE)
    assert np.all(cov_sum <= 1.0)


def test_matching_window() -> None:
    """Pairs too close (no triangulation) or too wide (no matches) cover less than a good one."""
    pts = grid_patch(0.0, half=0.02, n=3)[None]
    r = {a: coverage_reward(pair_at(1.5, a / 2), pts, NO_REGISTRATION, IMAGE) for a in (1, 15, 40, 60)}
    assert r[15] == pytest.approx(1.0, abs=1e-6)
    assert r[1] < 0.5 and r[60] == 0.0 and 0 < r[40] < r[15]
    # with the registration a pair in the window is one part of the model, which the ground
    # markers place: as without
    for a in (15, 40):
        assert coverage_reward(pair_at(1.5, a / 2), pts, ALL_ON, IMAGE) == pytest.approx(r[a], abs=1e-6)


def test_image_frustum_is_rectangular() -> None:
    """A point 42 degrees above the axis is inside the paper's 45-degree cone but outside the
    4:3 image (vertical half-FoV 36.9 degrees)."""
    cams = pair_at(1.0, 5.0, target=(0.0, 0.0, 1.0))
    p = np.array([[0.0, 0.0, 1.0 + math.tan(math.radians(42.0)) * 1.0]])[None]
    assert coverage_reward(cams, p, ALL_ON, IMAGE) == 0.0
    assert coverage_reward(cams, p, replace(ALL_ON, frustum=False, resolution=False), IMAGE) > 0.0


def test_wind_average_and_batches() -> None:
    rng = np.random.default_rng(1)
    R = rng.normal(size=(3, 400, 3)) * 0.2 + np.array([0, 0, 1.0])
    cams = np.stack([pair_at(2.0, 8.0), pair_at(3.0, 12.0), pair_at(1.5, 20.0)])
    batch = coverage_reward(cams, R, ALL_ON, IMAGE)
    per_k = np.array([[coverage_reward(c, R[k:k + 1], ALL_ON, IMAGE) for k in range(3)] for c in cams])
    np.testing.assert_allclose(batch, per_k.mean(axis=1), atol=1e-5)  # eq. 7: the mean over the winds
    small = coverage_reward(cams, R, ALL_ON, IMAGE, max_elements=1 << 12)  # chunked: the same values
    np.testing.assert_allclose(small, batch, atol=1e-5)


def test_degenerate_inputs() -> None:
    pts = grid_patch(0.0)[None]
    with pytest.raises(ValueError):
        coverage_reward(pair_at(2.0, 8.0)[:1], pts)
    with pytest.raises(ValueError):
        coverage_reward(pair_at(2.0, 8.0), np.zeros((1, 0, 3)))
    cams = pair_at(2.0, 8.0)
    cams[1, 3:] = 0.0  # a zero viewing vector sees nothing: no pair
    assert coverage_reward(cams, pts, ALL_ON, IMAGE) == 0.0
    on_point = look_at(pts[0, :2], [[1.0, 0.0, 1.0], [1.0, 0.1, 1.0]])
    assert np.isfinite(coverage_reward(on_point, pts, ALL_ON, IMAGE))


def ring_at(distance: float, azimuths_deg, target=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Cameras at ``distance`` from ``target`` at the given azimuths (level), looking at it."""
    t = np.asarray(target, float)
    a = np.radians(np.asarray(azimuths_deg, float))
    c = t + distance * np.stack([np.cos(a), np.sin(a), np.zeros(len(a))], axis=1)
    return look_at(c, np.broadcast_to(t, c.shape))


def blob(n: int = 400, seed: int = 0) -> np.ndarray:
    """A ball of points around (0, 0, 1), one realization (1, n, 3)."""
    return (np.random.default_rng(seed).normal(size=(n, 3)) * 0.15 + np.array([0.0, 0.0, 1.0]))[None]


def test_view_graph_of_two_tight_pairs_falls_apart_and_zeroes_the_reward() -> None:
    """coverage-graph: two stereo pairs a quarter turn apart share no matchable point (80+ degrees
    between them, the window ends at 30), so lambda_2 = 0 and the reward is 0, while coverage
    scores them well; the same four cameras on a 24-degree arc hang together and keep their
    coverage times min(1, lambda_2 / scale)."""
    pts = blob()
    params = replace(NO_REGISTRATION, view_graph=True)
    split = ring_at(2.0, [0, 8, 90, 98])
    arc = ring_at(2.0, [0, 8, 16, 24])
    E = view_graph(split, pts, params, IMAGE)
    assert E.shape == (4, 4) and np.allclose(E, E.T) and np.all(np.diag(E) == 0) and np.all((E >= 0) & (E <= 1))
    assert E[0, 1] > 0.1 and E[2, 3] > 0.1                        # inside a pair: many shared points
    assert np.all(E[:2, 2:] == 0)                                 # between the pairs: none
    assert view_graph_factor(torch.as_tensor(E)[None], 1e-3).item() == 0.0
    cov_split = coverage_reward(split, pts, NO_REGISTRATION, IMAGE)
    assert cov_split > 0.3 and coverage_reward(split, pts, params, IMAGE) == 0.0
    E_arc = torch.as_tensor(view_graph(arc, pts, params, IMAGE))[None]
    lam2 = torch.linalg.eigvalsh(torch.diag_embed(E_arc.sum(-1)) - E_arc)[0, 1].item()
    assert lam2 > 0
    for scale in (1e-9, 10 * lam2):                               # saturated; and a tenth of it
        want = coverage_reward(arc, pts, NO_REGISTRATION, IMAGE) * min(1.0, lam2 / scale)
        got = coverage_reward(arc, pts, replace(params, graph_scale=scale), IMAGE)
        assert got == pytest.approx(want, rel=1e-5)
    with pytest.raises(ValueError, match="graph_scale"):
        coverage_reward(arc, pts, replace(params, graph_scale=0.0), IMAGE)


def test_view_graph_links_a_second_sortie_to_the_cameras_flown() -> None:
    """With fixed cameras the graph spans both sorties: a new pair far from the flown pair scores
    0 under coverage-graph (it would register on its own), one beside it does not."""
    pts = blob()
    flown = ring_at(2.0, [0, 8])
    far, near = ring_at(2.0, [90, 98]), ring_at(2.0, [16, 24])
    fn = make_reward("coverage-graph", pts, fov=IMAGE.fov, image=IMAGE, fixed_cameras=flown)
    plain = make_reward(("coverage", CoverageParams(registration=False)), pts, fov=IMAGE.fov, image=IMAGE,
                        fixed_cameras=flown)
    got = fn(np.stack([far, near]))
    assert got[0] == 0.0 and plain(far[None])[0] > 0.3
    # the name decides: ("coverage-graph", params) keeps the view graph even if params leave it off
    named = make_reward(("coverage-graph", CoverageParams()), pts, fov=IMAGE.fov, image=IMAGE, fixed_cameras=flown)
    assert named(far[None])[0] == 0.0
    assert 0.0 < got[1] <= plain(near[None])[0] + 1e-12


def _skew(a: np.ndarray) -> np.ndarray:
    return np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])


def test_placement_error_is_the_similarity_fit_propagated_to_the_points() -> None:
    """sigma_i(p)^2 in closed form against the 7 x 7 information of the similarity (t, omega, s)
    fitted to the centres and attitudes, inverted and propagated with G(b) = [I, -[b]x, b];
    within_tau against scipy's chi(3) CDF; a part of one camera: inf."""
    from scipy.stats import chi

    rng = np.random.default_rng(3)
    c = rng.normal(size=(5, 3)) * [1.0, 0.5, 0.2] + [0, 0, 2]
    pts = rng.normal(size=(7, 3))
    sp, sa = 0.02, 0.5
    a = c - c.mean(0)
    J = [np.concatenate([np.eye(3), -_skew(x), x[:, None]], 1) for x in a]
    info = sum(j.T @ j for j in J) / sp ** 2
    info[3:6, 3:6] += len(c) * np.eye(3) / math.radians(sa) ** 2
    cov = np.linalg.inv(info)
    want = [np.trace(G @ cov @ G.T) for G in
            (np.concatenate([np.eye(3), -_skew(b), b[:, None]], 1) for b in pts - c.mean(0))]
    cams = torch.as_tensor(np.concatenate([c, -c], 1))[None]
    got = placement_error(cams, torch.ones(1, 5, 5, dtype=torch.bool), torch.as_tensor(pts), sp, sa)
    assert got.shape == (1, 5, 7) and np.allclose(got[0].numpy(), np.array(want)[None], rtol=1e-9)
    alone = placement_error(cams, torch.eye(5, dtype=torch.bool)[None], torch.as_tensor(pts), sp, sa)
    assert torch.isinf(alone).all()
    var = torch.tensor([1e-6, 1e-4, 4e-4, 1e-2, math.inf, 0.0])
    x = math.sqrt(3) * 0.02 / np.sqrt(var.numpy()[:4])
    assert np.allclose(within_tau(var, 0.02).numpy()[:4], chi.cdf(x, 3), atol=1e-7)
    assert within_tau(var, 0.02)[4] == 0.0 and within_tau(var, 0.02)[5] == 1.0


def test_a_model_in_two_parts_is_placed_worse_than_one() -> None:
    """Three cameras on each side of a plant (8 degrees apart; the sides share no point SIFT can
    match) make two parts (the pair rule), each placed on its own 0.3 m of baseline: the
    registration lowers their coverage, with ground markers too (they place the whole, not one
    part against the other). Six cameras on one 40-degree arc make one part: with markers the
    reward is coverage's; without them its placement counts too."""
    pts = blob()
    split = ring_at(2.0, [0, 8, 16, 180, 188, 196])
    arc = ring_at(2.0, [0, 8, 16, 24, 32, 40])
    E = torch.as_tensor(view_graph(split, pts, ALL_ON, IMAGE))[None]
    same = model_parts(E, 1e-3)[0]
    assert same[:3, :3].all() and same[3:, 3:].all() and not same[:3, 3:].any()
    plain = {k: coverage_reward(c, pts, NO_REGISTRATION, IMAGE) for k, c in (("split", split), ("arc", arc))}
    reg = {k: coverage_reward(c, pts, ALL_ON, IMAGE) for k, c in (("split", split), ("arc", arc))}
    bare = {k: coverage_reward(c, pts, replace(ALL_ON, ground_control=False), IMAGE)
            for k, c in (("split", split), ("arc", arc))}
    assert plain["split"] > 0.5 and reg["split"] < 0.8 * plain["split"] and bare["split"] < reg["split"]
    assert reg["arc"] == pytest.approx(plain["arc"], abs=1e-6) and bare["arc"] < plain["arc"]
    assert reg["arc"] > reg["split"]
