"""bench/bench_real.py (issue 41, part 4): its first pass, its prior, its ranking with failures last
and its table, on stand-ins (the benchmark itself reconstructs for an hour)."""
from __future__ import annotations

import numpy as np

from bench import bench_real as br


def ring(m: int, start: float = 0.0) -> np.ndarray:
    a = start + 2 * np.pi * np.arange(m) / m
    c = np.stack([0.3 * np.cos(a) + 0.375, 0.3 * np.sin(a) + 0.375, np.full(m, 0.08)], axis=1)
    return np.concatenate([c, np.array([0.375, 0.375, -0.03]) - c], axis=1)  # looking down at the plant


def test_the_first_pass_is_evenly_spaced_about_what_the_views_look_at() -> None:
    cams = ring(60)[np.random.default_rng(0).permutation(60)]
    assert np.allclose(br.look_at_point(cams), [0.375, 0.375, -0.03], atol=1e-9)
    pos = np.round(np.degrees(np.arctan2(cams[:, 1] - 0.375, cams[:, 0] - 0.375)) / 6).astype(int) % 60
    chosen = np.sort(pos[br.first_pass_views(cams)])
    assert len(chosen) == 12 and set(np.diff(chosen).tolist()) == {5}


def test_the_prior_keeps_the_plant_not_the_specks() -> None:
    rng = np.random.default_rng(0)
    plant = np.stack([0.005 * rng.standard_normal(2000), 0.005 * rng.standard_normal(2000),
                      rng.uniform(0, 0.4, 2000)], axis=1)
    speck = rng.normal([0.3, 0.0, 0.1], 0.01, (60, 3))  # a cloth fold the first pass kept
    keep = br.clean_prior(np.concatenate([plant, speck]))
    assert len(keep) == 2000 and keep.max() < 2000


def test_failures_rank_last_and_the_bar_and_table() -> None:
    assert br.spearman_of([0.9, 0.8, 0.7, 0.1], [1.0, 2.0, 3.0, None]) == 1.0
    assert br.spearman_of([0.1, 0.8, 0.7, 0.9], [1.0, 2.0, 3.0, None]) < 0
    plans = [{'n': 6, 'method': 'egp', 'reward': 0.8, 'chamfer': 0.4, 'shape': 0.3, 'registered': 6},
             {'n': 6, 'method': 'circle', 'reward': 0.1, 'chamfer': None, 'error': 'RECONSTRUCTION_FAILED',
              'error_msg': 'none of the 40 sparse points lies on plant pixels'},
             {'n': 6, 'method': 'random subset', 'reward': 0.5, 'chamfer': 1.0, 'shape': 0.8, 'registered': 6},
             {'n': 6, 'method': 'random subset', 'reward': 0.3, 'chamfer': None, 'error': 'NOTHING_VISIBLE',
              'error_msg': 'x'}]
    a = br.analyse(plans, [6])
    assert a['by_n']['6']['egp_at_most_circle'] is True and a['failed'] == 2
    assert a['spearman_reward_vs_minus_chamfer'] > 0.9
    assert a['by_n']['6']['random']['chamfer']['failed'] == 1 and a['by_n']['6']['random']['failures'] == \
        ['NOTHING_VISIBLE']
    data = {'scan': 's', 'views': 60, 'image_size': [1440, 1080], 'reference': {'registered': 60, 'points': 9},
            'prior': {'views': list(range(12)), 'registered': 12, 'points_kept': 5, 'points_first_pass': 6},
            'evaluations': 100, 'reward_model': 'coverage', 'ns': [6], 'random': 2, 'plans': plans, 'analysis': a}
    md = br.markdown(data)
    assert '| 6 | egp | 0.800 | 6 / 6 | 0.40 | 0.30 |' in md and '| 6 | circle | 0.100 | RECONSTRUCTION_FAILED |' in md
    assert '| 6 | 2 random subsets | - | 1 failed | 1.00 +- - (n=1) |' in md and 'N=6 yes' in md
