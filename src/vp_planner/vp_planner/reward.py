"""The paper's geometric reconstruction reward (Bacharis et al., eqs. 2-7), vectorized.

A plan z = [x_1, ..., x_N] holds N cameras x_i = [c_i, v_i] (position c_i, viewing direction
v_i, not necessarily unit). For a point cloud {p} of P points (eq. 2)::

    r(z; p_1..p_P) = 1/(P S) * sum_p sum_{i<j} f(c_i, c_j; p) g(c_i, v_i, c_j, v_j; p)

with S = N (N - 1) / 2 unordered camera pairs and

    f = |(c_i - p) x (c_j - p)| / (|c_i - p| |c_j - p|)                 (eq. 4)
      = sin(phi_2^{ij}),  the sine of the angle between the two rays at p
    g = 1(cond_1^i) 1(cond_1^j) 1(cond_2^{ij})                           (eq. 5)
    cond_1^i    : cos(phi_1^i) - cos(FoV / 2) >= 0                        (eq. 6, first)
    cond_2^{ij} : cos(phi_2^{ij}) - cos(theta_match) >= 0                 (eq. 6, second)
    cos(phi_2^{ij}) = (c_i - p).(c_j - p) / (|c_i - p| |c_j - p|)

**Physical reading of cond_1 (deliberate deviation from the paper's literal text).** The
paper writes cos(phi_1^i) = (c_i - p).v_i / (|c_i - p| |v_i|), which is the cosine between the
viewing direction and the vector from the point *to* the camera, i.e. it would declare visible
what lies *behind* the camera. We use the physical reading: p is in view of camera i when the
angle between v_i and the ray from the camera to the point, p - c_i, is at most FoV/2::

    cos(phi_1^i) = (p - c_i).v_i / (|p - c_i| |v_i|) >= cos(FoV / 2).

f and cond_2 use c_i - p and c_j - p as written (their sign convention does not matter there).

The noisy reward (eq. 7) is the mean of r over K realizations of the noisy scene (paper
Sec. V-A: "the average reward function value of the five distinct noisy environments"). Since
every realization holds the same number P of points, that mean equals r evaluated on the union
of the K*P points, which is how :func:`noisy_reward` computes it.

Degenerate inputs never produce NaN or inf: a camera exactly on a point does not see that point,
a zero (or non-finite) viewing vector sees nothing, and coincident cameras give f = 0.

Implementation (memory traffic dominates, so the layout matters). Every quantity the reward
needs is an affine function of (p, |p|^2), so matrix products of coefficient rows with
[p, |p|^2, 1] produce them all::

    |p - c_i|^2          = |p|^2 - 2 p.c_i + |c_i|^2
    (p - c_i).v_i        = p.v_i - c_i.v_i
    (p - c_i).(p - c_j)  = |p|^2 - p.(c_i + c_j) + c_i.c_j

Coordinates are first centred on the point cloud's centroid to limit cancellation. Then, per
camera, 1/|p - c_i| and the visibility mask; per pair, cos(phi_2) = (p - c_i).(p - c_j) /
(|p - c_i| |p - c_j|) and f = sqrt(max(0, 1 - cos^2)). An invisible point gets a zero inverse
distance, so that its cos(phi_2) is 0 and fails cond_2 without a separate mask (when
theta_match < pi/2). The work is split into chunks of plans, blocks of points and blocks of
camera pairs so that no intermediate array exceeds about ``max_elements`` elements (8 MB in
float64 by default) whatever N: the memory of one call is that bound plus O(S) for the pairs'
indices and accumulators (N = 1000 cameras would otherwise need 80 GB at once).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

__all__ = ["reward", "noisy_reward", "PreparedPoints", "prepare_points", "DEFAULT_FOV", "DEFAULT_THETA_MATCH"]

DEFAULT_FOV: float = math.pi / 2
DEFAULT_THETA_MATCH: float = math.pi / 4

#: Bound on the number of elements of the largest intermediate array of one chunk.
DEFAULT_MAX_ELEMENTS: int = 1 << 20


def _as_tensor(x: Any, dtype: torch.dtype) -> torch.Tensor:
    if isinstance(x, torch.Tensor):
        return x.detach().to(device="cpu", dtype=dtype)
    return torch.as_tensor(np.asarray(x), dtype=dtype)


def _resolve_dtype(dtype: Any) -> torch.dtype:
    if dtype is None or dtype in ("float64", "double", np.float64, torch.float64):
        return torch.float64
    if dtype in ("float32", "float", np.float32, torch.float32):
        return torch.float32
    raise ValueError(f"dtype must be float64 or float32, got {dtype!r}")


def _check_angles(fov: float, theta_match: float) -> None:
    if not (math.isfinite(fov) and 0.0 < fov <= 2.0 * math.pi):
        raise ValueError(f"fov must be in (0, 2*pi], got {fov}")
    if not (math.isfinite(theta_match) and 0.0 <= theta_match <= math.pi):
        raise ValueError(f"theta_match must be in [0, pi], got {theta_match}")


@dataclass(frozen=True)
class PreparedPoints:
    """A point cloud laid out for :func:`_reward_core` (reusable across calls).

    p_aug = [x, y, z, |p|^2, 1]^T (5, P) of the points centred on ``centre`` (the centroid of the
    finite points), ``scale2`` = max |p - centre|^2 over the finite points. ``weights`` (P,) or
    None: point weights w_p of the weighted eq. 2 (see :func:`prepare_points`).
    """

    p_aug: torch.Tensor
    centre: torch.Tensor
    scale2: float
    num_points: int
    weights: "torch.Tensor | None" = None

    @classmethod
    def of(cls, pts: torch.Tensor, weights: "torch.Tensor | None" = None) -> "PreparedPoints":
        dtype = pts.dtype
        P = pts.shape[0]
        if bool(torch.isfinite(pts).all()):
            centre = pts.mean(dim=0)
            p = pts - centre
            sq = (p * p).sum(dim=1, keepdim=True)
            scale2 = float(sq.max())
        else:
            finite = torch.isfinite(pts).all(dim=1)
            centre = pts[finite].mean(dim=0) if bool(finite.any()) else torch.zeros(3, dtype=dtype)
            p = pts - centre
            sq = (p * p).sum(dim=1, keepdim=True)
            scale2 = float(sq[finite].max()) if bool(finite.any()) else 1.0
        p_aug = torch.cat([p, sq, torch.ones(P, 1, dtype=dtype)], dim=1).T.contiguous()
        return cls(p_aug, centre, scale2, P, weights)


def _reward_core(
    cams: torch.Tensor,
    prep: PreparedPoints,
    fov: float,
    theta_match: float,
    max_elements: int,
    point_block: int = 65536,
) -> torch.Tensor:
    """r for cams (B, N, 6) and prepared points (both of the working dtype); returns (B,)."""
    B, N, _ = cams.shape
    P = prep.num_points
    dtype = cams.dtype
    S = N * (N - 1) // 2
    out = torch.zeros(B, dtype=dtype)
    if B == 0:
        return out

    # Centre on the centroid of the (finite) points: the reward is translation invariant.
    p_aug = prep.p_aug
    c = cams[..., :3] - prep.centre  # (B, N, 3)
    v = cams[..., 3:]  # (B, N, 3)

    # Per-camera validity: finite position and a non-zero finite viewing vector.
    v_norm = torch.linalg.vector_norm(v, dim=-1)  # (B, N)
    cam_ok = torch.isfinite(c).all(-1) & torch.isfinite(v).all(-1) & (v_norm > 0)
    c = torch.where(cam_ok[..., None], c, torch.zeros((), dtype=dtype))
    v = torch.where(cam_ok[..., None], v, torch.zeros((), dtype=dtype))
    inv_vn = torch.where(cam_ok, 1.0 / torch.where(cam_ok, v_norm, torch.ones((), dtype=dtype)), torch.zeros((), dtype=dtype))
    # cond_1 threshold; +inf for an invalid camera (it sees nothing).
    thr = torch.where(cam_ok, torch.full((), math.cos(fov / 2.0), dtype=dtype), torch.full((), math.inf, dtype=dtype))

    ii, jj = torch.triu_indices(N, N, offset=1)
    cos_match = math.cos(theta_match)
    wts = prep.weights
    # eq. 2 with point weights w_p: 1 / (S sum_p w_p) sum_p w_p sum_{i<j} f g (w_p = 1: the paper's)
    denom = float(P * S) if wts is None else float(S) * max(float(wts.sum()), 1e-300)
    # A camera closer than this to a point does not see it (the direction is undefined).
    eps = torch.finfo(dtype).eps
    scale2 = max(prep.scale2, float((c * c).sum(-1).max()), 1e-300)
    tol_r2 = 64.0 * eps * scale2

    # Coefficient rows (per plan), columns matching p_aug's rows [x, y, z, |p|^2, 1]: N rows for
    # |p - c_i|^2 and N rows for (p - c_i).v_i here; the S pair rows for (p - c_i).(p - c_j) are
    # built per block of pairs below.
    cc = (c * c).sum(-1)  # (B, N)
    cv = (c * v).sum(-1)  # (B, N)
    one = torch.ones(B, N, 1, dtype=dtype)
    zero = torch.zeros(B, N, 1, dtype=dtype)
    rows_r2 = torch.cat([-2.0 * c, one, cc[..., None]], dim=-1)  # (B, N, 5)
    rows_dv = torch.cat([v, zero, -cv[..., None]], dim=-1)  # (B, N, 5)
    cam_coeff = torch.cat([rows_r2, rows_dv], dim=1)  # (B, 2N, 5)

    # Block sizes: every intermediate array holds at most about max_elements elements: per block
    # of pb points, the camera terms (2N x pb) and one block of sb pairs (sb x pb) at a time.
    # Several plans share a chunk only when all their rows fit at once (small N).
    pb = max(1, min(P, int(point_block), max_elements // (2 * N)))
    sb = max(1, min(S, max_elements // pb))
    chunk = max(1, int(max_elements // max(1, (2 * N + S) * pb))) if sb >= S else 1
    zero = torch.zeros((), dtype=dtype)
    # With cos(theta_match) > 0 an invisible point can be encoded as a zero inverse distance:
    # then cos(phi_2) = 0 < cos(theta_match) and the pair drops out of eq. 5 without a mask.
    fold_visibility = cos_match > 0.0
    for b0 in range(0, B, chunk):
        b1 = min(B, b0 + chunk)
        nb = b1 - b0
        cb = c[b0:b1]
        cf = cam_coeff[b0:b1].reshape(nb * 2 * N, 5)
        ivn = inv_vn[b0:b1, :, None]
        th = thr[b0:b1, :, None]
        pair_blocks = []  # (first pair, i indices, j indices, coefficient rows (k nb, 5))
        distinct = torch.empty(nb, S, dtype=dtype)  # coincident cameras: f = 0 exactly
        for s0 in range(0, S, sb):
            a, b = ii[s0:s0 + sb], jj[s0:s0 + sb]
            csum = cb[:, a] + cb[:, b]  # (nb, k, 3)
            cdot = (cb[:, a] * cb[:, b]).sum(-1)  # (nb, k)
            rows = torch.cat([-csum, torch.ones(nb, len(a), 1, dtype=dtype), cdot[..., None]], dim=-1)
            pair_blocks.append((s0, a, b, rows.reshape(nb * len(a), 5)))
            distinct[:, s0:s0 + len(a)] = (cb[:, a] != cb[:, b]).any(dim=-1).to(dtype)
        acc = torch.zeros(nb, S, dtype=dtype)
        for p0 in range(0, P, pb):
            pts = p_aug[:, p0 : p0 + pb]
            q = torch.mm(cf, pts).view(nb, 2 * N, -1)
            r2 = q[:, :N]  # |p - c_i|^2
            cos1 = q[:, N:]  # (p - c_i).v_i, turned into cos(phi_1^i) in place
            inv_r = torch.rsqrt(r2.clamp_min(tol_r2))  # 1 / |p - c_i|, finite everywhere
            cos1 *= inv_r
            cos1 *= ivn
            # cond_1 (eq. 6, physical reading): (p - c_i).v_i / (|p - c_i| |v_i|) >= cos(FoV/2);
            # a camera on the point (or a non-finite distance) does not see it.
            vis = (cos1 >= th) & (r2 > tol_r2)  # (nb, N, pb)
            if fold_visibility:
                w = torch.where(vis, inv_r, zero)
            else:
                vis &= inv_r > 0  # |p - c_i|^2 overflowed: no direction
            for s0, a, b, rows in pair_blocks:
                dd = torch.mm(rows, pts).view(nb, len(a), -1)  # (p - c_i).(p - c_j)
                if fold_visibility:
                    cos2 = w[:, a]
                    cos2 *= w[:, b]
                    cos2 *= dd  # cos(phi_2^{ij}); 0 where either camera does not see p
                    g = cos2 >= cos_match  # eq. 5: cond_1^i cond_1^j cond_2^{ij}
                else:
                    cos2 = inv_r[:, a]
                    cos2 *= inv_r[:, b]
                    cos2 *= dd
                    g = vis[:, a] & vis[:, b] & (cos2 >= cos_match)
                # eq. 4: f = |a x b| / (|a||b|) = sin(phi_2) = sqrt(1 - cos^2(phi_2))
                f = cos2.square_().neg_().add_(1.0).clamp_min_(0.0).sqrt_()
                fg = torch.where(g, f, zero)
                if wts is not None:
                    fg *= wts[p0:p0 + pb]
                acc[:, s0:s0 + len(a)] += fg.sum(dim=2)
        # Coincident cameras: f = 0 exactly (sqrt(1 - cos^2) would leave ~1e-8 of round-off).
        out[b0:b1] = (acc * distinct).sum(dim=1) / denom  # eq. 2: 1 / (P S) sum_p sum_{i<j} f g
    return out


def prepare_points(points: Any, dtype: Any = torch.float64, weights: Any = None) -> PreparedPoints:
    """Lay out a (P, 3) cloud, or (K, P, 3) realizations (flattened, see :func:`noisy_reward`),
    once for repeated :func:`reward` / :func:`noisy_reward` calls (pass it as ``points``).

    ``weights``: None (the paper's eq. 2), or one weight w_p >= 0 a point, of the points' shape
    without the last axis ((P,) or (K, P)); the reward is then the weighted mean over points,
    1 / (S sum_p w_p) sum_p w_p sum_{i<j} f g (a second sortie weighs points already
    reconstructed less, README "A second sortie")."""
    dt = _resolve_dtype(dtype)
    pts = _as_tensor(points, dt)
    w = None if weights is None else _as_tensor(weights, dt)
    if w is not None and tuple(w.shape) != tuple(pts.shape[:-1]):
        raise ValueError(f"weights must have shape {tuple(pts.shape[:-1])} (one a point), got {tuple(w.shape)}")
    if w is not None and not (bool(torch.isfinite(w).all()) and bool((w >= 0).all())):
        raise ValueError("point weights must be finite and >= 0")
    if pts.ndim == 3 and pts.shape[-1] == 3:
        pts = pts.reshape(-1, 3)
    if pts.ndim != 2 or pts.shape[-1] != 3:
        raise ValueError(f"points must have shape (P, 3), got {tuple(pts.shape)}")
    if pts.shape[0] == 0:
        raise ValueError("the point cloud is empty")
    return PreparedPoints.of(pts, None if w is None else w.reshape(-1))


def _prepare(cameras: Any, points: Any, dtype: torch.dtype) -> tuple[torch.Tensor, PreparedPoints, tuple[int, ...]]:
    cams = _as_tensor(cameras, dtype)
    if isinstance(points, PreparedPoints):
        if points.p_aug.dtype != dtype:
            raise ValueError(f"prepared points are {points.p_aug.dtype}, the computation is {dtype}")
        prep = points
        pts = None
    else:
        pts = _as_tensor(points, dtype)
    if cams.ndim < 2 or cams.shape[-1] != 6:
        raise ValueError(f"cameras must have shape (..., N, 6), got {tuple(cams.shape)}")
    N = cams.shape[-2]
    if N < 2:
        raise ValueError(f"the reward needs at least 2 cameras (pairs), got N = {N}")
    if pts is not None:
        if pts.ndim != 2 or pts.shape[-1] != 3:
            raise ValueError(f"points must have shape (P, 3), got {tuple(pts.shape)}")
        if pts.shape[0] == 0:
            raise ValueError("the point cloud is empty")
        prep = PreparedPoints.of(pts)
    batch_shape = tuple(cams.shape[:-2])
    return cams.reshape(-1, N, 6), prep, batch_shape


def _finish(out: torch.Tensor, batch_shape: tuple[int, ...], like: Any) -> Any:
    out = out.reshape(batch_shape)
    if isinstance(like, torch.Tensor):
        return out
    arr = out.numpy()
    return arr if batch_shape else float(arr)


def reward(
    cameras: Any,
    points: Any,
    fov: float = DEFAULT_FOV,
    theta_match: float = DEFAULT_THETA_MATCH,
    *,
    dtype: Any = torch.float64,
    max_elements: int = DEFAULT_MAX_ELEMENTS,
) -> Any:
    """Paper eq. 2: r(z; p_1..p_P) for a batch of plans.

    Args:
        cameras: (..., N, 6) rows [cx, cy, cz, vx, vy, vz], N >= 2; numpy or torch.
        points: (P, 3) point cloud, P >= 1, or a :class:`PreparedPoints` of the same dtype.
        fov: full field of view (rad) of cond_1 (eq. 6); p is seen by camera i when the angle
            between v_i and p - c_i is <= fov / 2 (physical reading, see module docstring).
        theta_match: largest angle between c_i - p and c_j - p for cond_2 (eq. 6).
        dtype: torch.float64 (default) or torch.float32 for the computation.
        max_elements: bound on the elements of one chunk's intermediate arrays.

    Returns:
        Rewards of shape ``cameras.shape[:-2]`` in [0, 1]: a torch tensor (of ``dtype``) for torch
        input, a numpy array otherwise (a Python float for a single (N, 6) plan).
    """
    _check_angles(fov, theta_match)
    dt = _resolve_dtype(dtype)
    cams, prep, batch_shape = _prepare(cameras, points, dt)
    out = _reward_core(cams, prep, fov, theta_match, max_elements)
    return _finish(out, batch_shape, cameras)


def noisy_reward(cameras: Any, realizations: Any, fov: float = DEFAULT_FOV,
                 theta_match: float = DEFAULT_THETA_MATCH, **options: Any) -> Any:
    """Paper eq. 7: r~(z) = (1/K) sum_k r(z; p~^(k)_1..p~^(k)_P), the mean over K realizations.

    Args:
        cameras: (..., N, 6) plans as in :func:`reward`.
        realizations: (K, P, 3) noisy point clouds (a (P, 3) array counts as K = 1), or
            ``prepare_points(realizations)``.
        fov, theta_match, options: as :func:`reward` (its keywords ``dtype`` and ``max_elements``).

    Because each realization has the same P points, the mean of the K rewards equals the
    reward of the K*P points taken together, which is what is computed (one pass).
    """
    R = realizations
    if isinstance(R, PreparedPoints):
        return reward(cameras, R, fov, theta_match, **options)
    if isinstance(R, torch.Tensor):
        flat = R.reshape(-1, R.shape[-1]) if R.ndim == 3 else R
    else:
        R = np.asarray(R)
        flat = R.reshape(-1, R.shape[-1]) if R.ndim == 3 else R
    if R.ndim not in (2, 3) or R.shape[-1] != 3:
        raise ValueError(f"realizations must have shape (K, P, 3), got {tuple(R.shape)}")
    return reward(cameras, flat, fov, theta_match, **options)
