"""Shared fixtures of the vp_planner tests: a synthetic, corn-like noisy scene."""
from __future__ import annotations

import numpy as np
import pytest
import torch

# As the planner node and CLI do by default: one torch thread, the other core for the rest.
torch.set_num_threads(1)


def synthetic_plant(n: int = 1500, seed: int = 0) -> np.ndarray:
    """A cylinder-ish plant about 2 m tall: a stalk plus leaves spreading out with height."""
    rng = np.random.default_rng(seed)
    n_stalk = n // 4
    z_s = rng.uniform(0.0, 2.0, n_stalk)
    stalk = np.stack([0.02 * rng.normal(size=n_stalk), 0.02 * rng.normal(size=n_stalk), z_s], axis=1)
    n_leaf = n - n_stalk
    z_l = rng.uniform(0.2, 1.9, n_leaf)
    r_l = rng.uniform(0.0, 1.0, n_leaf) * (0.15 + 0.3 * np.sin(np.pi * z_l / 2.0))
    a_l = rng.choice(np.linspace(0, 2 * np.pi, 8, endpoint=False), n_leaf) + 0.2 * rng.normal(size=n_leaf)
    leaves = np.stack([r_l * np.cos(a_l), r_l * np.sin(a_l), z_l - 0.2 * r_l], axis=1)
    return np.concatenate([stalk, leaves])


def wind_realizations(points: np.ndarray, k: int = 3, levels: int = 10, variance: float = 0.002,
                      seed: int = 0) -> np.ndarray:
    """(K, P, 3): the paper's wind model, level l of a point shifted by l * n_wind along +x."""
    rng = np.random.default_rng(seed)
    z = points[:, 2]
    lev = np.clip(np.ceil((z - z.min()) / (np.ptp(z) + 1e-12) * levels), 1, levels)
    out = []
    for _ in range(k):
        q = points.copy()
        q[:, 0] += lev * rng.normal(0.0, np.sqrt(variance))
        out.append(q)
    return np.stack(out)


@pytest.fixture(scope="session")
def plant_points() -> np.ndarray:
    return synthetic_plant()


@pytest.fixture(scope="session")
def realizations(plant_points: np.ndarray) -> np.ndarray:
    return wind_realizations(plant_points)


@pytest.fixture(scope="session")
def small_realizations() -> np.ndarray:
    """A 500-point plant in 2 wind realizations: a small, real reward problem for BO tests."""
    return wind_realizations(synthetic_plant(500, seed=1), k=2)


@pytest.fixture(scope="session")
def plant_row():
    """A factory: realizations (K, P, 3) of synthetic plants standing at x = xs (y = 0), and the
    plant of every point (P,)."""
    def make(xs, n: int = 300, k: int = 2) -> tuple[np.ndarray, np.ndarray]:
        plants = [synthetic_plant(n, seed=i) + np.array([x, 0.0, 0.0]) for i, x in enumerate(xs)]
        return wind_realizations(np.concatenate(plants), k=k), np.repeat(np.arange(len(xs)), n)
    return make
