"""Planning a field by parts: EGP-VP in 48-96 dimensions by decomposition.

A plan of N cameras is a point of a 6N-dimensional space; with 8-16 drones over a field of 9-12
plants that is 48-96 dimensions, where a GP fitted on a hundred or so evaluations models next to
nothing (``bench/bench_fields.py`` compares plain EGP-EI with planning by parts). Planning by parts:

1. **partition** the field into G parts: k-means (Lloyd, k-means++ seeding; scipy's ``kmeans2``)
   on the horizontal positions of the scene points, parts numbered along the field's principal
   axis. No plant identities are needed: the planner sees only the noisy point cloud;
2. **allocate** the N cameras to the parts in proportion to their points (largest remainder),
   at least 2 per part (a pair);
3. **plan each part** with EGP-EI (or GP-EI) in its own 6 n_g dimensions, on its own points:
   its reward is the reconstruction of that part, its cameras keep the stand-off from every
   plant of the field and the separation from the cameras of the parts planned before it;
4. **the whole field**: the field's structured plans (rings, arcs, caps about all its points) are
   scored on the whole field's reward too: part plans each good on their own part can make a
   model that falls apart (a part's cameras share no point with the next part's), which the
   reward's registration term scores low (:mod:`vp_planner.reward_models`);
5. **refine jointly**: the better of the union of the part plans and the best structured plan
   (each camera put into a part's shell, :func:`vp_planner.bo_planning._in_parts`) is the
   incumbent of a trust-region EGP-EI on the whole field's reward, each camera parameterized in
   its own part's shell (:class:`JointSpace`), so that cameras can trade coverage across part
   boundaries.

How many parts (:func:`auto_parts`): one per :data:`CAMERAS_PER_PART` cameras (4, the paper's
one-plant N), but parts no narrower than :data:`MIN_PART_SIZE` along the field's longest
horizontal side (so a single plant is never cut in two), and 1 (no decomposition) for the
paper's scenarios (N <= 6 there).
"""
from __future__ import annotations

from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray

from .space import ViewSpace

__all__ = ["CAMERAS_PER_PART", "MIN_PART_SIZE", "auto_parts", "partition", "allocate_cameras", "JointSpace"]

#: Cameras per part that :func:`auto_parts` aims at.
CAMERAS_PER_PART: int = 4
#: Smallest extent (m) of a part along the field's longest horizontal side (a Corn50 plant's
#: leaves spread 1.5-1.9 m: a single plant is never split).
MIN_PART_SIZE: float = 1.2
#: Points k-means is run on (a seeded subsample of the first realization).
_KMEANS_POINTS = 5000


def auto_parts(realizations: NDArray[np.float64], num_cameras: int) -> int:
    """G = min(floor(N / 4), floor(L / 1.2 m)), at least 1, L the longest horizontal side of the
    field's bounding box (all realizations)."""
    flat = np.asarray(realizations, dtype=np.float64).reshape(-1, 3)
    side = float(np.max(flat[:, :2].max(axis=0) - flat[:, :2].min(axis=0)))
    return max(1, min(int(num_cameras) // CAMERAS_PER_PART, int(side // MIN_PART_SIZE)))


def partition(realizations: NDArray[np.float64], parts: int, seed: int = 0) -> NDArray[np.int64]:
    """Part label (P,) of every scene point: k-means with ``parts`` centres on the horizontal
    positions of the first realization (the same point in every realization belongs to the same
    plant, so one labelling serves all K). Parts are numbered in order along the principal axis
    of their centres, towards +x (+y for a field along y). Raises ValueError when a part would be
    empty."""
    R = np.asarray(realizations, dtype=np.float64)
    xy = R[0, :, :2]
    G = int(parts)
    if G < 1 or G > len(xy):
        raise ValueError(f"parts must be from 1 to the number of points ({len(xy)}), got {parts}")
    if G == 1:
        return np.zeros(len(xy), dtype=np.int64)
    from scipy.cluster.vq import kmeans2

    rng = np.random.default_rng([seed, 7])
    sub = xy[rng.choice(len(xy), size=min(len(xy), _KMEANS_POINTS), replace=False)]
    centres, _ = kmeans2(sub, G, minit="++", seed=np.random.default_rng([seed, 8]))
    labels = np.argmin(((xy[:, None, :] - centres[None]) ** 2).sum(-1), axis=1)
    rel = centres - centres.mean(axis=0)
    axis = np.linalg.svd(rel, full_matrices=False)[2][0]
    if axis[0] < -1e-9 or (abs(axis[0]) <= 1e-9 and axis[1] < 0):
        axis = -axis          # the sign of a singular vector is arbitrary: number parts towards +x (+y)
    rank = np.empty(G, dtype=np.int64)
    rank[np.argsort(rel @ axis, kind="stable")] = np.arange(G)
    labels = rank[labels]
    sizes = np.bincount(labels, minlength=G)
    if np.any(sizes == 0):
        raise ValueError(f"cannot cut the field into {G} parts: a part has no points (sizes {sizes.tolist()})")
    return labels


def allocate_cameras(sizes: Any, num_cameras: int, minimum: int = 2) -> NDArray[np.int64]:
    """Cameras per part (G,), summing to N: ``minimum`` each, the rest in proportion to ``sizes``
    (points per part) by the largest-remainder rule. ValueError when N < minimum * G."""
    sizes = np.asarray(sizes, dtype=np.float64)
    G, N = len(sizes), int(num_cameras)
    if G < 1 or np.any(sizes <= 0):
        raise ValueError(f"part sizes must be positive, got {sizes.tolist()}")
    if N < minimum * G:
        raise ValueError(f"{N} cameras cannot give {G} parts {minimum} cameras each")
    counts = np.full(G, minimum, dtype=np.int64)
    share = sizes / sizes.sum() * (N - counts.sum())
    counts += np.floor(share).astype(np.int64)
    left = N - int(counts.sum())
    counts[np.argsort(-(share - np.floor(share)), kind="stable")[:left]] += 1
    return counts


class JointSpace:
    """The parameterization of the joint refinement: camera block g (``dims[g]`` coordinates) is
    decoded by part g's :class:`ViewSpace` (its shell and look-at box); feasibility and reward
    are the whole field's (``full``: all points, all N cameras). Quacks like a ViewSpace for
    :class:`vp_planner.space.Objective` and :func:`vp_planner.bo.optimize`."""

    def __init__(self, full: ViewSpace, parts: list) -> None:
        if sum(p.num_cameras for p in parts) != full.num_cameras:
            raise ValueError("the parts' cameras must add up to the full plan's")
        self.full, self.parts = full, list(parts)
        self.num_cameras, self.dim, self.realizations = full.num_cameras, full.dim, full.realizations

    def decode(self, U: Any) -> Any:
        """Plans (B, N, 6) (or (N, 6) for a vector) from U (B, 6N): block g by part g's space."""
        is_torch = isinstance(U, torch.Tensor)
        X = U.detach().cpu().to(torch.float64).numpy() if is_torch else np.asarray(U, dtype=np.float64)
        single = X.ndim == 1
        X = np.atleast_2d(X)
        out, a = [], 0
        for p in self.parts:
            out.append(np.asarray(p.decode(X[:, a:a + p.dim])).reshape(X.shape[0], p.num_cameras, 6))
            a += p.dim
        cams = np.concatenate(out, axis=1)
        cams = cams[0] if single else cams
        return torch.from_numpy(cams) if is_torch else cams

    def _feasible_cameras(self, cams: NDArray[np.float64]) -> NDArray[np.bool_]:
        return self.full._feasible_cameras(cams)

    def feasible(self, U: Any) -> Any:
        """Feasibility (B,) of U (B, 6N) under the whole field's rules (torch in, torch out)."""
        is_torch = isinstance(U, torch.Tensor)
        cams = np.asarray(self.decode(U.detach().cpu().numpy() if is_torch else U)).reshape(-1, self.num_cameras, 6)
        ok = self._feasible_cameras(cams)
        return torch.from_numpy(ok) if is_torch else ok

    def reward(self, cams: Any, dtype: torch.dtype = torch.float64) -> Any:
        """The whole field's reward (eq. 7) of plans (..., N, 6)."""
        return self.full.reward(cams, dtype)

    @property
    def periodic(self) -> NDArray[np.bool_]:
        return np.concatenate([p.periodic for p in self.parts])

